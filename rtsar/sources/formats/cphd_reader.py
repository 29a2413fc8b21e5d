"""Read a CPHD file (NGA.STND.0068-1, 1.0.1 or 1.1.0) into rtsar's shots, with sarkit's reader.

The subset rtsar's geometry covers: one FX-domain channel with fixed frequency sampling and a
straight track at a constant step.  A file rtsar wrote (``rtsar export --cphd``) carries its
processing configuration (ProductInfo parameter ``rtsar:config``) and reads back into the very
shots it was made of; for any other file a configuration is derived from the PVPs
(rtsar.sources.formats.cphd_geometry).  The signal vectors go back to shots through the inverse
of rtsar.sources.formats.phase_history; anything else (TOA domain, several channels, a curved
track) is refused in one line.  A spotlight recording rtsar exported (its scene holds the
spotlight geometry, rtsar.spot) is read back with its arc checked against that geometry and its
other channels (the bistatic receiver, ``rtsar:channels``) as auxiliary channels.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ...params import C_M_PER_S, config_from_dict
from ...spot.geometry import geometry_from_dict
from .cphd_geometry import SPOT_CHANNELS_PARAMETER, channel_config, derived_config, spot_to_local_m
from .foreign import ForeignRecording, telemetry_problem
from .geometry import EAST_HEADING_DEG, LocalFrame, platform_height_m
from .phase_history import fx_mapping, fx_to_shots
from .requirements import require_formats
from .timebase import parse_utc

try:
    import sarkit.cphd as skcphd
except ImportError:  # the optional extra "formats"
    skcphd = None


def srp_delay_s(pvp, srp_range_m: float) -> np.ndarray:
    """Each vector's two-way delay to its SRP minus 2 R_c / c (float64[vector]), from the PVPs
    (the exporter and the reader compute it alike, from the same stored numbers)."""
    tx = np.linalg.norm(pvp["TxPos"] - pvp["SRPPos"], axis=-1)
    rcv = np.linalg.norm(pvp["RcvPos"] - pvp["SRPPos"], axis=-1)
    return (tx + rcv - 2.0 * srp_range_m) / C_M_PER_S


SPOT_KEY = "spotlight"  # a spotlight recording's scene: {"spotlight": SpotScene.to_dict()}
SPOT_ARC_TOLERANCE_M = 1e-6  # the stored positions against the arc of the recorded geometry


def spot_geometry_of(scene: dict | None, path):
    """The spotlight geometry (rtsar.spot.geometry) a recording's scene carries; None for a
    strip-map recording; ValueError naming ``path`` when it does not parse."""
    spot = (scene or {}).get(SPOT_KEY)
    if not isinstance(spot, dict) or "spotlight_geometry" not in spot:
        return None
    try:
        return geometry_from_dict(spot["spotlight_geometry"])
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


class _FxShots:
    """The shots of one CPHD channel, read and transformed block by block on slicing."""

    def __init__(self, reader, channel: str, mapping, vectors: int, dtau_s: np.ndarray):
        self._reader, self._channel, self._m, self._n = reader, channel, mapping, vectors
        self._dtau = dtau_s

    def __len__(self) -> int:
        return self._n

    @property
    def shape(self) -> tuple[int, int]:
        return (self._n, self._m.samples_per_shot)

    def __getitem__(self, key) -> np.ndarray:
        if not isinstance(key, slice) or key.step not in (None, 1):
            raise TypeError("CPHD shots are read in contiguous blocks")
        start, stop, _ = key.indices(self._n)
        if stop <= start:
            return np.zeros((0, self._m.samples_per_shot), np.complex64)
        fx = self._reader.read_signal(self._channel, start_vector=start, stop_vector=stop)
        return fx_to_shots(self._m, fx, self._dtau[start:stop])


def _parameters(tree) -> dict:
    return {
        p.get("name"): p.text or "" for p in tree.getroot().findall("./{*}ProductInfo/{*}Parameter")
    }


def _described_bytes(path: Path) -> int:
    """The end of the last block the CPHD file header (``KEY := VALUE`` lines up to the form
    feed; NGA.STND.0068-1 §3) places: what a complete file holds at least."""
    with open(path, "rb") as f:
        head = f.read(8192).split(b"\f", 1)[0].decode("ascii", "replace")
    fields = dict(
        (k.strip(), v.strip()) for k, _, v in (line.partition(":=") for line in head.splitlines())
    )
    ends = [0]
    for block in ("XML", "PVP", "SIGNAL", "SUPPORT"):
        offset, size = fields.get(f"{block}_BLOCK_BYTE_OFFSET"), fields.get(f"{block}_BLOCK_SIZE")
        if offset and size and offset.isdigit() and size.isdigit():
            ends.append(int(offset) + int(size))
    return max(ends)


def open_cphd(path: str | Path) -> ForeignRecording:
    """Open a CPHD file as a recording; ValueError naming the file and what rtsar cannot read."""
    require_formats(skcphd, "reading CPHD")
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path}: no such file")
    f = open(path, "rb")
    try:
        # A truncated file (an interrupted copy) is refused here, by its size, not mid-run.
        need, have = _described_bytes(path), path.stat().st_size
        if have < need:
            raise ValueError(
                f"the file holds {have} bytes; its header describes {need} (cut short?)"
            )
        try:
            reader = skcphd.Reader(f)
        except Exception as exc:  # sarkit raises several kinds on a file that is not CPHD
            raise ValueError(f"not a CPHD file ({exc})") from None
        tree = reader.metadata.xmltree
        root = tree.getroot()
        if root.findtext("./{*}Global/{*}DomainType") != "FX":
            raise ValueError("only FX-domain CPHD is read (this one is TOA domain)")
        fmt = root.findtext("./{*}Data/{*}SignalArrayFormat")
        if fmt != "CF8":  # CI2/CI4 hold integers scaled per vector (AmpSF): not read here
            raise ValueError(
                f"SignalArrayFormat {fmt}: rtsar reads CF8 (complex float) signal arrays only"
            )
        if root.find("./{*}Data/{*}SignalCompressionID") is not None:
            raise ValueError("a compressed signal array (SignalCompressionID): not read")
        channels = root.findall("./{*}Data/{*}Channel")
        params = _parameters(tree)
        scene = json.loads(params.get("rtsar:scene", "{}") or "{}")
        spot = spot_geometry_of(scene, path) if "rtsar:config" in params else None
        mode = (root.findtext("./{*}CollectionID/{*}RadarMode/{*}ModeType") or "").strip()
        if mode == "SPOTLIGHT" and spot is None and "rtsar:config" in params:
            raise ValueError(
                "a spotlight collection (RadarMode SPOTLIGHT) written by rtsar whose rtsar:scene "
                "has no spotlight geometry: it is not imaged without it"
            )
        if len(channels) != 1 and spot is None:
            raise ValueError(f"{len(channels)} channels: rtsar reads one-channel CPHD")
        ref_id = root.findtext("./{*}Channel/{*}RefChId")
        channels.sort(key=lambda c: c.findtext("./{*}Identifier") != ref_id)  # reference first
        channel = channels[0].findtext("./{*}Identifier")
        pvp = reader.read_pvps(channel)
        vectors = len(pvp)
        derived = None
        if mode not in ("STRIPMAP", "SPOTLIGHT"):
            raise ValueError(
                f"RadarMode ModeType {mode}: rtsar images STRIPMAP collections (and the "
                "SPOTLIGHT ones it wrote), not this one"
            )
        if "rtsar:config" in params:  # written by rtsar: its own configuration
            cfg = config_from_dict(json.loads(params["rtsar:config"]))
            check_tx_rcv(root, cfg)
            if mode != ("SPOTLIGHT" if spot is not None else "STRIPMAP"):
                raise ValueError(
                    f"RadarMode ModeType {mode} contradicts its rtsar:scene (a "
                    f"{'spotlight' if spot is not None else 'strip-map'} collection): the file "
                    "was changed after rtsar wrote it"
                )
        else:  # made elsewhere: a configuration from the collection's geometry
            derived = derived_config(pvp, int(channels[0].findtext("./{*}NumSamples")))
            cfg = derived[0]
        m = fx_mapping(cfg)
        if int(channels[0].findtext("./{*}NumSamples")) != m.num_samples:
            raise ValueError(
                f"{m.num_samples} samples per vector expected from the configuration, "
                f"the file has {channels[0].findtext('./{*}NumSamples')}"
            )
        if vectors and not (
            np.allclose(pvp["SC0"], m.sc0_hz, rtol=1e-12, atol=1e-3)
            and np.allclose(pvp["SCSS"], m.scss_hz, rtol=1e-9)
        ):
            raise ValueError("SC0/SCSS differ from the configuration's frequency sampling")
        notes = []
        if derived is None:
            check_band(root, channel, pvp, m)
            lat, lon = (float(v) for v in params.get("rtsar:origin_lat_lon_deg", "0,0").split(","))
            heading = float(params.get("rtsar:heading_deg", EAST_HEADING_DEG))
            local = LocalFrame(lat, lon, heading).from_ecf(pvp["TxPos"])
            if spot is None:
                notes += track_note(path, cfg, local)
        else:
            local = derived[2]
        aux, along = {}, local[:, 0]
        if spot is not None:
            along, aux = _spot_channels(reader, channels, params, spot, cfg, local, vectors)
        names = pvp.dtype.names
        index = (
            np.asarray(pvp["rtsar_pulse_index"], np.int64)
            if "rtsar_pulse_index" in names
            else np.arange(vectors, dtype=np.int64)
        )
        time_s = np.asarray(pvp["TxTime"], np.float64)
        problem = telemetry_problem(cfg, index, along)
        if problem:
            raise ValueError(problem)
        start = float(along[0])  # the derived frame: x = 0 abeam of the middle vector's SRP
        if derived is None:
            start = float(params.get("rtsar:start_along_track_m", start))
        position = local if cfg.geometry.platform_height_m > 0 else None
        collection_start = _collection_start(root, params)
    except (ValueError, KeyError, TypeError) as exc:
        f.close()
        raise ValueError(f"{path}: {exc}") from None
    return ForeignRecording(
        path,
        cfg,
        scene,
        vectors,
        start,
        _FxShots(reader, channel, m, vectors, srp_delay_s(pvp, m.srp_range_m)),
        index,
        time_s,
        aux,
        position if spot is None else None,
        f.close,
        collection_start,
        notes,
    )


def _collection_start(root, params: dict):
    """Global/Timeline/CollectionStart as naive UTC; None where rtsar wrote it without knowing
    it (``rtsar:collection_start_utc`` "unknown")."""
    if params.get("rtsar:collection_start_utc") == "unknown":
        return None
    return parse_utc(root.findtext("./{*}Global/{*}Timeline/{*}CollectionStart"), "CollectionStart")


TX_RCV_TOLERANCE = 1e-9  # relative: the XML holds 17 significant digits


def check_tx_rcv(root, cfg) -> None:
    """The chirp and receiver TxRcv declares (rtsar.sinks.exports.cphd.tx_rcv) against the
    file's own rtsar:config: a file edited or damaged since is refused, naming the field."""
    tx, rcv = root.find("./{*}TxRcv/{*}TxWFParameters"), root.find("./{*}TxRcv/{*}RcvParameters")
    if tx is None or rcv is None:
        return  # written before TxRcv was: nothing declared to check
    wf = cfg.waveform
    fmcw = wf.kind == "fmcw"
    length = wf.chirp_duration_s if fmcw else wf.pulse_duration_s
    for node, name, want in (
        (tx, "PulseLength", length),
        (tx, "RFBandwidth", wf.bandwidth_hz),
        (tx, "FreqCenter", cfg.geometry.carrier_hz),
        (tx, "LFMRate", wf.chirp_rate_hz_per_s),
        (rcv, "WindowLength", length if fmcw else wf.receive_window_s),
        (rcv, "SampleRate", wf.sample_rate_hz),
    ):
        text = node.findtext(f"./{{*}}{name}")
        value = float(text) if text is not None else float("nan")
        if not abs(value - want) <= TX_RCV_TOLERANCE * abs(want):
            raise ValueError(
                f"TxRcv {name} {text} contradicts its rtsar:config ({want!r}): the file was "
                "changed after rtsar wrote it"
            )


def check_band(root, channel: str, pvp, m) -> None:
    """The band a file rtsar wrote declares (its channel's FxC and FxBW, per-vector FX1/FX2)
    against the FX mapping of its rtsar:config, which the processor uses: a file edited since
    is refused, naming the field."""
    params = [
        p
        for p in root.findall("./{*}Channel/{*}Parameters")
        if p.findtext("./{*}Identifier") == channel
    ]
    declared = []
    if params:
        for name, want in (("FxC", m.fxc_hz), ("FxBW", m.fx2_hz - m.fx1_hz)):
            text = params[0].findtext(f"./{{*}}{name}")
            declared.append((f"Channel {name}", text, want))
    for name, want in (("FX1", m.fx1_hz), ("FX2", m.fx2_hz)):
        values = np.asarray(pvp[name], np.float64)
        worst = values[np.argmax(np.abs(values - want))] if len(values) else want
        declared.append((f"the PVP {name}", repr(float(worst)), want))
    for name, text, want in declared:
        try:
            value = float(text)
        except (TypeError, ValueError):
            value = float("nan")
        if not abs(value - want) <= TX_RCV_TOLERANCE * abs(want):
            raise ValueError(
                f"{name} {text} Hz contradicts its rtsar:config ({want!r} Hz, the band rtsar "
                "processes): the file was changed after rtsar wrote it"
            )


TRACK_NOTE_M = 1e-3  # TxPos off the configured track by more than this (rms) is said


def track_note(path, cfg, local: np.ndarray) -> list[str]:
    """A line (in a list; none if on track) where a strip-map file's TxPos leave the straight
    track of its rtsar:config, (x, 0, h): rtsar images that track, never these positions."""
    r_c = cfg.processor.range_centre_m or cfg.geometry.slant_range_m
    h = platform_height_m(r_c, cfg.geometry.platform_height_m)
    off = np.hypot(local[:, 1], local[:, 2] - h) if len(local) else np.zeros(0)
    rms = float(np.sqrt(np.mean(off**2))) if len(off) else 0.0
    if not rms > TRACK_NOTE_M:
        return []
    return [
        f"{path}: TxPos leaves the straight track of its rtsar:config by {rms:.3g} m rms "
        f"(at most {float(off.max()):.3g} m) across track and in height: rtsar images the "
        "configured track, not these positions"
    ]


def _spot_channels(reader, channels, params: dict, spot, cfg, local, vectors: int):
    """(along-arc positions as the recording's ``along_track_m``, auxiliary channels) of a
    spotlight CPHD rtsar wrote: the reference channel's TxPos must lie on the recorded arc
    (within SPOT_ARC_TOLERANCE_M), every other channel is read with its own LO delay."""
    if vectors != spot.pulses:
        raise ValueError(f"{vectors} vectors, the spotlight geometry plans {spot.pulses}")
    arc = spot_to_local_m(spot.station_m())
    off = float(np.abs(local - arc).max()) if vectors else 0.0
    if off > SPOT_ARC_TOLERANCE_M:
        raise ValueError(f"TxPos leaves the recorded spotlight arc by {off:.3g} m")
    known = json.loads(params.get(SPOT_CHANNELS_PARAMETER, "{}") or "{}")
    aux = {}
    for c in channels[1:]:
        ident = c.findtext("./{*}Identifier")
        if ident not in known:
            raise ValueError(
                f"channel {ident!r} is not one rtsar wrote ({SPOT_CHANNELS_PARAMETER})"
            )
        m = fx_mapping(channel_config(cfg, known[ident]["reference_range_m"]))
        pvp = reader.read_pvps(ident)
        if len(pvp) != vectors:
            raise ValueError(f"channel {ident!r} holds {len(pvp)} vectors, not {vectors}")
        aux[known[ident]["name"]] = _FxShots(
            reader, ident, m, vectors, srp_delay_s(pvp, m.srp_range_m)
        )
    return spot.range_m * spot.angles_rad(), aux  # R₀θ_n, as rtsar spot-simulate records it
