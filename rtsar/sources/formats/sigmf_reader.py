"""Read a SigMF recording (sigmf.org, 1.x) as rtsar shots, with the sigmf package.

The layout rtsar.sinks.exports.sigmf_export writes: ``cf32_le`` samples, shots of
``rtsar:samples_per_shot`` one after the other, one capture per shot (its receive window:
``core:sample_start`` = p·S, ``core:datetime`` its UTC time where the recording kept its
collection start), the processing configuration in ``rtsar:config`` (or, for a recording made
elsewhere, a configuration given by the caller), one annotation per shot with
``rtsar:pulse_index`` / ``rtsar:time_s``, and the auxiliary channels listed in
``rtsar:channels``.  The recording is the ``.sigmf-meta``/``.sigmf-data`` pair or a SigMF
archive (``.sigmf``, rtsar.sources.formats.sigmf_store).  The samples are memory-mapped, never
converted: shots come back bit for bit.

Everything the metadata declares is checked against what it describes before any work, and a
file that contradicts itself is refused in one line naming the field: the sample rate, PRF and
chirp against ``rtsar:config``; captures (at least one, at shot boundaries, in order, their
``core:datetime`` at their shots' ``rtsar:time_s``); the
per-shot annotations (one per shot in an rtsar export, numbers and times finite); a spotlight
export's station positions without the spotlight geometry they belong to.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ...params import config_from_dict
from .foreign import ForeignRecording, telemetry_problem
from .requirements import require_formats
from .sigmf_store import ARCHIVE, COMPRESSED_ARCHIVES, DATA, META, Archive, SideBySide, sigmf_base
from .timebase import parse_utc, shifted

try:
    from sigmf import sigmffile
except ImportError:  # the optional extra "formats"
    sigmffile = None

RTSAR_EXTENSION = {"name": "rtsar", "version": "1.0.0", "optional": True}
DECLARED_TOLERANCE = 1e-9  # relative, between a declared figure and rtsar:config's
SPOT_KEY = "spotlight"  # a spotlight recording's scene (rtsar.sources.formats.cphd_reader)


def locate(path) -> tuple[object, str]:
    """(where the files are, the recording's name) of a SigMF file name: an archive (its one
    main recording) or the base name of a metadata/data pair."""
    path = Path(path)
    if path.name.lower().endswith((ARCHIVE, *COMPRESSED_ARCHIVES)) and path.is_file():
        store = Archive(path)
        mains = [n for n in store.names() if _global_of(store, n).get("rtsar:channel") is None]
        if len(mains) != 1:
            raise ValueError(
                f"{path}: an archive of {len(mains)} recordings ({', '.join(mains) or 'none'}): "
                "rtsar reads one recording (and its channels) per archive"
            )
        return store, mains[0]
    base = sigmf_base(path) or path
    return SideBySide(base.parent), base.name


def _global_of(store, name: str) -> dict:
    try:
        g = json.loads(store.meta_text(name)).get("global")
    except (ValueError, AttributeError):
        return {}
    return g if isinstance(g, dict) else {}


def _load(store, name: str):
    """(global, captures, annotations) of one recording's metadata, schema-checked."""
    meta = store.describe(name, META)
    text = store.meta_text(name)
    try:
        _check_shape(json.loads(text))
        handle = sigmffile.SigMFFile(metadata=text, skip_checksum=True)
        handle.validate()
    except Exception as exc:  # sigmf raises its own error kinds on a malformed file
        raise ValueError(f"{meta}: not SigMF metadata ({_schema_words(exc)})") from None
    g = handle.get_global_info()
    if g.get("core:datatype") != "cf32_le":
        raise ValueError(f"{meta}: core:datatype {g.get('core:datatype')!r}, rtsar reads cf32_le")
    if g.get("core:num_channels", 1) != 1:
        raise ValueError(f"{meta}: interleaved channels are not read (one channel per file)")
    return g, handle.get_captures(), handle.get_annotations()


def _check_shape(meta) -> None:
    """The object SigMF metadata is: ``global`` an object, ``captures`` and ``annotations``
    lists of objects (ValueError naming the key; the sigmf package fails on them with an
    AttributeError that names none)."""
    if not isinstance(meta, dict):
        raise ValueError(f"the metadata is a JSON {type(meta).__name__}, not an object")
    if not isinstance(meta.get("global"), dict):
        raise ValueError("'global' is missing or not an object")
    for key in ("captures", "annotations"):
        items = meta.get(key, [])
        if not isinstance(items, list):
            raise ValueError(f"{key!r} is a {type(items).__name__}, not a list of objects")
        wrong = [k for k, item in enumerate(items) if not isinstance(item, dict)]
        if wrong:
            kind = type(items[wrong[0]]).__name__
            raise ValueError(f"{key}[{wrong[0]}] is a {kind}, not an object")


def _schema_words(exc: Exception) -> str:
    """One line of what is wrong: a schema error (jsonschema) names where, in short."""
    where = getattr(exc, "absolute_path", None)
    message = getattr(exc, "message", None) or str(exc).strip() or type(exc).__name__
    message = message.splitlines()[0]
    if " does not match '" in message:  # a pattern too long to be read: the value alone
        message = message.split(" does not match '")[0] + " is not of the form SigMF requires"
    if where:
        path = "".join(f"[{p}]" if isinstance(p, int) else f"[{p!r}]" for p in where)
        return f"at {path}: {message}"
    return message


def _shots(samples: np.ndarray, width, what) -> np.ndarray:
    if not isinstance(width, int) or isinstance(width, bool) or width < 1:
        raise ValueError(f"{what}: samples_per_shot {width!r} is not a whole number >= 1")
    if samples.size % width:
        raise ValueError(f"{what}: {samples.size} samples are not whole shots of {width}")
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


def _finite(name: str, value) -> float:
    """``value`` if it is a finite number, else ValueError naming it."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not (ok and math.isfinite(value)):
        raise ValueError(f"{name} {value!r} is not a finite number")
    return float(value)


def _same(name: str, declared, expected: float) -> None:
    """A declared figure must be a finite number equal to the configuration's."""
    if abs(_finite(name, declared) - expected) > DECLARED_TOLERANCE * abs(expected):
        raise ValueError(f"{name} {declared!r} contradicts rtsar:config ({expected!r})")


def check_declared(g: dict, captures: list, cfg) -> None:
    """The global and capture fields an rtsar export declares, against ``cfg``."""
    wf, geo = cfg.waveform, cfg.geometry
    if "core:sample_rate" in g:
        _same("core:sample_rate", g["core:sample_rate"], wf.sample_rate_hz)
    if "rtsar:prf_hz" in g:
        _same("rtsar:prf_hz", g["rtsar:prf_hz"], geo.prf_hz)
    if "rtsar:carrier_hz" in g:
        _same("rtsar:carrier_hz", g["rtsar:carrier_hz"], geo.carrier_hz)
    chirp = g.get("rtsar:chirp")
    if chirp is not None:
        if not isinstance(chirp, dict) or chirp.get("kind") != wf.kind:
            raise ValueError(f"rtsar:chirp {chirp!r} is not the configuration's {wf.kind} chirp")
        duration = wf.chirp_duration_s if wf.kind == "fmcw" else wf.pulse_duration_s
        for key, want in (
            ("bandwidth_hz", wf.bandwidth_hz),
            ("duration_s", duration),
            ("rate_hz_per_s", wf.chirp_rate_hz_per_s),
        ):
            _same(f"rtsar:chirp {key}", chirp.get(key), want)
    for c in captures:
        if "core:frequency" in c:
            _same("the capture's core:frequency", c["core:frequency"], geo.carrier_hz)


def _capture_starts(captures: list, width: int, pulses: int) -> list[int]:
    """The shots where the captures begin: at least one capture, each at a shot boundary, in
    order, inside the data."""
    if not captures:
        raise ValueError("no capture: SigMF needs one at least (its sample 0)")
    starts = [c.get("core:sample_start") for c in captures]
    if any(not isinstance(s, int) or isinstance(s, bool) or s < 0 for s in starts):
        raise ValueError("a capture's core:sample_start is not a sample number")
    if starts[0] != 0 or any(b <= a for a, b in zip(starts, starts[1:], strict=False)):
        raise ValueError("the captures must start at sample 0 and in order")
    if any(s % width for s in starts):
        raise ValueError(f"a capture starts inside a shot (shots are {width} samples)")
    if pulses and starts[-1] >= pulses * width:
        raise ValueError(f"a capture starts at sample {starts[-1]}, past the data's end")
    return [s // width for s in starts]


def _per_shot(annotations: list, pulses: int, width: int, ours: bool, cfg):
    """(pulse_index, time_s, the annotations in shot order) from the per-shot annotations."""
    per_shot = [a for a in annotations if "rtsar:pulse_index" in a]
    if not per_shot:
        if ours and pulses:  # an rtsar export writes one per shot: these were lost
            raise ValueError(
                f"{pulses} shots and no rtsar:pulse_index annotation (an rtsar "
                "export has one per shot: the metadata lost them)"
            )
        index = np.arange(pulses, dtype=np.int64)
        return index, index / cfg.geometry.prf_hz, []
    if len(per_shot) != pulses:
        raise ValueError(f"{len(per_shot)} shot annotations for {pulses} shots")
    per_shot.sort(key=lambda a: a["core:sample_start"])
    if [a["core:sample_start"] for a in per_shot] != list(range(0, pulses * width, width)):
        raise ValueError("the shot annotations do not start at the shots' first samples")
    for p, a in enumerate(per_shot):  # the shot's extent: its boundaries depend on it
        if a.get("core:sample_count", width) != width:
            raise ValueError(
                f"shot {p}'s annotation has core:sample_count {a['core:sample_count']!r}; "
                f"its shots are {width} samples (the shot boundaries are unknown)"
            )
    raw = [a["rtsar:pulse_index"] for a in per_shot]
    if not all(isinstance(v, int) and not isinstance(v, bool) and abs(v) < 1 << 63 for v in raw):
        raise ValueError("an rtsar:pulse_index is not a whole number")
    for p, a in enumerate(per_shot):
        _finite(f"shot {p}'s rtsar:time_s", a.get("rtsar:time_s"))
    time_s = np.array([a["rtsar:time_s"] for a in per_shot], np.float64)
    return np.array(raw, np.int64), time_s, per_shot


def _column(per_shot: list, key: str, shape: tuple) -> np.ndarray | None:
    """A per-shot annotation field as float64 [pulse, *shape] (None where absent)."""
    if not per_shot or key not in per_shot[0]:
        return None
    try:
        values = np.array([a.get(key) for a in per_shot], np.float64)
    except (TypeError, ValueError):
        values = np.zeros(0)
    if values.shape != (len(per_shot), *shape) or not np.isfinite(values).all():
        raise ValueError(f"{key} is not {shape or 'one'} finite number(s) in every shot")
    return values


CAPTURE_TIME_TOLERANCE_S = 2e-6  # core:datetime holds microseconds: two roundings


def _capture_times(captures: list, first_shots: list, time_s, timed: bool):
    """The collection start (UTC of time_s = 0) from the captures' ``core:datetime``, None where
    the first has none.  Every capture's time is checked: with per-shot ``rtsar:time_s``
    (``timed``) it must be the collection start + its first shot's time (a file whose times
    disagree contradicts itself); without, the captures' times must increase."""
    if not captures or not len(time_s) or captures[0].get("core:datetime") is None:
        return None
    at = [
        None
        if c.get("core:datetime") is None
        else parse_utc(c["core:datetime"], f"capture {k}'s core:datetime")
        for k, c in enumerate(captures)
    ]
    start = shifted(at[0], -float(time_s[first_shots[0]]))
    for k in range(1, len(captures)):
        if at[k] is None:
            continue
        seconds = (at[k] - start).total_seconds()
        if timed and abs(seconds - time_s[first_shots[k]]) > CAPTURE_TIME_TOLERANCE_S:
            raise ValueError(
                f"capture {k}'s core:datetime {captures[k]['core:datetime']} is "
                f"{seconds!r} s after the collection start; its shot {first_shots[k]}'s "
                f"rtsar:time_s says {float(time_s[first_shots[k]])!r} s"
            )
        previous = next((t for t in at[k - 1 :: -1] if t is not None), at[0])
        if not timed and at[k] <= previous:
            raise ValueError(
                f"capture {k}'s core:datetime {captures[k]['core:datetime']} is not after the "
                "capture before it: the captures' times must increase"
            )
    return start


def open_sigmf(path: str | Path, config=None) -> ForeignRecording:
    """Open a SigMF recording; ``config`` (rtsar.params.Config) where it carries none."""
    require_formats(sigmffile, "reading SigMF")
    store, name = locate(path)
    meta = store.describe(name, META)
    g, captures, annotations = _load(store, name)
    main = auxiliary_of(g, Path(name))
    if main is not None:
        raise ValueError(
            f"{meta} holds the auxiliary channel {g['rtsar:channel']!r} of a SigMF "
            f"export, not a recording: give its recording, {store.describe(main.name, META)}"
        )
    try:
        ours = "rtsar:config" in g
        if ours:
            cfg = config_from_dict(g["rtsar:config"])
        elif config is not None:
            cfg = config
        else:
            raise ValueError(
                "no rtsar:config in the global object: rtsar reads the SigMF recordings that "
                "carry their configuration (`rtsar export --sigmf` writes it)"
            )
        check_declared(g, captures, cfg)
        width = g.get("rtsar:samples_per_shot", cfg.waveform.samples_per_shot)
        if width != cfg.waveform.samples_per_shot:
            raise ValueError(
                f"shots of {width!r} samples; the configuration's waveform has "
                f"{cfg.waveform.samples_per_shot}"
            )
        shots = _shots(store.samples(name), width, store.describe(name, DATA))
        pulses = len(shots)
        first_shots = _capture_starts(captures, width, pulses)
        index, time_s, per_shot = _per_shot(annotations, pulses, width, ours, cfg)
        start = _finite("rtsar:start_along_track_m", g.get("rtsar:start_along_track_m", 0.0))
        along = _column(per_shot, "rtsar:along_track_m", ())
        if along is None:
            along = start + cfg.geometry.along_track_step_m * np.arange(pulses)
        problem = telemetry_problem(cfg, index, along)
        if problem:
            raise ValueError(problem)
        position = _column(per_shot, "rtsar:position_m", (3,))
        scene = json.loads(json.dumps(g.get("rtsar:scene") or {}))
        if not isinstance(scene, dict):
            raise ValueError("rtsar:scene is not a JSON object")
        station = _column(per_shot, "rtsar:station_position_m", (3,))
        if station is not None and not isinstance(scene.get(SPOT_KEY), dict):
            raise ValueError(
                "the shots carry spotlight station positions but rtsar:scene has no spotlight "
                "geometry: a spotlight recording is not imaged without it"
            )
        channels = _channels(store, name, g, pulses)
        collection_start = _capture_times(captures, first_shots, time_s, bool(per_shot))
        provenance = g.get("rtsar:provenance", {})  # (rtsar.sinks.exports.sigmf_export)
        if not isinstance(provenance, dict):
            raise ValueError("rtsar:provenance is not a JSON object")
    except (ValueError, KeyError, TypeError, OverflowError, AttributeError) as exc:
        raise ValueError(f"{meta}: {exc}") from None
    return ForeignRecording(
        Path(path),
        cfg,
        scene,
        pulses,
        start,
        shots,
        index,
        time_s,
        channels,
        position,
        collection_start=collection_start,
        attrs=dict(provenance),  # JSON values, as the export wrote them
    )


def _channels(store, name: str, g: dict, pulses: int) -> dict:
    """The auxiliary channels ``rtsar:channels`` lists, each a recording beside the main one."""
    listed = g.get("rtsar:channels", [])
    if not isinstance(listed, list) or not all(isinstance(c, dict) for c in listed):
        raise ValueError("rtsar:channels is not a list of {name, file, samples_per_shot}")
    channels = {}
    for c in listed:
        file, width = c.get("file"), c.get("samples_per_shot")
        if not isinstance(file, str) or not isinstance(c.get("name"), str):
            raise ValueError(f"rtsar:channels entry {c!r} has no name or file")
        _load(store, file)  # its metadata: cf32_le, one channel
        channels[c["name"]] = _shots(store.samples(file), width, store.describe(file, DATA))
        if len(channels[c["name"]]) != pulses:
            raise ValueError(f"channel {c['name']!r} holds another number of shots")
    return channels
