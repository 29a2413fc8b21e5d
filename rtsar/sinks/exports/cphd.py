"""Export a recording as a CPHD 1.0.1 file (NGA.STND.0068-1, Compensated Phase History Data).

Written with sarkit's CPHD writer (the NGA reference implementation); rtsar supplies only the
mapping.  One channel, FX domain (Global/SGN = -1): each shot becomes one signal vector by the
exact, invertible transform of rtsar.sources.formats.phase_history (pulsed: range compressed in
the frequency domain by a phase-only matched filter; FMCW: the dechirped samples), referenced to
a scene reference point (SRP) on the swath's centre line, broadside of the platform (per-vector
SRPPos).  Per-vector parameters: every one CPHD 1.0.1 requires (TxTime, TxPos, TxVel, RcvTime,
RcvPos, RcvVel, SRPPos, aFDOP, aFRR1, aFRR2, FX1, FX2, TOA1, TOA2, TDTropoSRP, SC0, SCSS) from
the recording's telemetry (``position_m`` where recorded, else the configuration's straight
track; stop-and-hop as in rtsar's signal model: RcvPos = TxPos), plus the added PVP
``rtsar_pulse_index``.  ReferenceGeometry is computed by sarkit from the PVPs.  The recording's
configuration and scene travel in ProductInfo parameters ``rtsar:config`` / ``rtsar:scene`` so
that rtsar reads the file back into the very same shots (rtsar.sources.formats.cphd_reader).
A strip-map recording's auxiliary channels (interferometric receivers, reference
interferometers) are left out, and the summary names them (the .h5 and the SigMF export keep
them).

A spotlight recording (rtsar.spot, Crouch ch. 9) is written on its own geometry: RadarMode
SPOTLIGHT, the SRP fixed at the scene centre, TxPos = RcvPos = the station on its arc
P_n = -R₀(sin θ_n, cos θ_n, 0) per vector (rtsar.sources.formats.cphd_geometry places the
collection plane through the scene centre at the local origin, tilted 30° so that the station
is above ground), so |TxPos - SRP| = R₀ at
every vector; the fixed bistatic receiver, when recorded, is a second CPHD channel
``rtsar-bistatic`` with TxPos on the arc, RcvPos = B and its own LO delay (ProductInfo
``rtsar:channels`` maps identifiers to rtsar channels and their LO ranges).
"""

from __future__ import annotations

import datetime
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ... import __version__
from ...params import C_M_PER_S
from ...sources.formats.cphd_geometry import (
    SPOT_CHANNELS_PARAMETER,
    channel_config,
    spot_station_local,
    spot_to_local_m,
)
from ...sources.formats.cphd_reader import spot_geometry_of, srp_delay_s
from ...sources.formats.geometry import LocalFrame, platform_height_m, platform_positions_m
from ...sources.formats.phase_history import FxMapping, fx_mapping, shots_to_fx
from ...sources.formats.requirements import require_formats
from ...spot.pfa import PolarFormatPlan
from ..io import replace_when_complete

try:
    import lxml.etree as etree
    import sarkit.cphd as skcphd
    import sarkit.wgs84 as skwgs84
except ImportError:  # the optional extra "formats": the CLI says how to install it
    skcphd = None

CPHD_NS = "http://api.nsgreg.nga.mil/schema/cphd/1.0.1"
CHANNEL = "rtsar-main"
# (name, words of 8 bytes, format): the PVP layout, in the order CPHD 1.0.1 lists them.
PVP_LAYOUT = [
    ("TxTime", 1, "F8"),
    ("TxPos", 3, "X=F8;Y=F8;Z=F8;"),
    ("TxVel", 3, "X=F8;Y=F8;Z=F8;"),
    ("RcvTime", 1, "F8"),
    ("RcvPos", 3, "X=F8;Y=F8;Z=F8;"),
    ("RcvVel", 3, "X=F8;Y=F8;Z=F8;"),
    ("SRPPos", 3, "X=F8;Y=F8;Z=F8;"),
    ("aFDOP", 1, "F8"),
    ("aFRR1", 1, "F8"),
    ("aFRR2", 1, "F8"),
    ("FX1", 1, "F8"),
    ("FX2", 1, "F8"),
    ("TOA1", 1, "F8"),
    ("TOA2", 1, "F8"),
    ("TDTropoSRP", 1, "F8"),
    ("SC0", 1, "F8"),
    ("SCSS", 1, "F8"),
]
ADDED_PVP = ("rtsar_pulse_index", 1, "I8")


def collection_geometry(rec, frame: LocalFrame) -> dict:
    """Per-pulse platform positions and velocities (local frame) of a recording, and the scene
    reference point (SRP): on the swath's centre line (slant range R_c at closest approach),
    abeam of the middle of the image."""
    cfg = rec.config
    geo = cfg.geometry
    r_c = cfg.processor.range_centre_m or geo.slant_range_m
    along = rec.start_along_track_m + geo.along_track_step_m * np.arange(rec.pulses)
    h = platform_height_m(r_c, geo.platform_height_m)
    pos = platform_positions_m(along, h, rec.position_m)
    if rec.pulses > 1:
        vel = np.gradient(pos, np.asarray(rec.time_s, np.float64), axis=0)
    else:
        vel = np.array([[geo.speed_mps, 0.0, 0.0]])
    if np.any(pos[:, 2] >= r_c):
        raise ValueError("the platform is higher than the centre range: no ground to image")
    n = cfg.processor.aperture_pulses
    x_first = rec.start_along_track_m + 0.5 * (n - 1) * geo.along_track_step_m
    x_last = rec.start_along_track_m + (rec.pulses - 1 - 0.5 * (n - 1)) * geo.along_track_step_m
    x_c = 0.5 * (x_first + x_last)
    y_c = float(np.sqrt(r_c**2 - h**2))
    srp = np.array([x_c, y_c, 0.0])
    return {
        "pos": pos,
        "vel": vel,
        "srp": srp,
        "height_m": h,
        "range_centre_m": r_c,
        "x_first": x_first,
        "x_last": x_last,
    }


@dataclass(frozen=True, eq=False)
class ExportChannel:
    """One CPHD channel: its rtsar channel, shots, FX mapping and per-vector geometry (local)."""

    identifier: str
    name: str  # "main" or the recording's auxiliary channel
    shots: object  # [pulse, sample] array-like that slices into blocks
    mapping: FxMapping
    tx_m: np.ndarray  # [pulse, 3]
    tx_vel: np.ndarray
    rcv_m: np.ndarray
    rcv_vel: np.ndarray
    srp_m: np.ndarray  # [3]
    reference_range_m: float | None  # the channel's LO delay as a one-way range (FMCW)

    def dtau_s(self, frame: LocalFrame) -> np.ndarray:
        """Each vector's SRP delay minus τ_c, from the ECF positions the PVPs will hold."""
        pv = {
            "TxPos": frame.to_ecf(self.tx_m),
            "RcvPos": frame.to_ecf(self.rcv_m),
            "SRPPos": frame.to_ecf(self.srp_m)[None, :],
        }
        return srp_delay_s(pv, self.mapping.srp_range_m)


def _strip_collection(rec, frame: LocalFrame):
    """(channels, SceneCoordinates, Dwell, mode, left out) of a strip-map recording."""
    g = collection_geometry(rec, frame)
    m = fx_mapping(rec.config)
    ch = ExportChannel(
        CHANNEL,
        "main",
        rec.shots,
        m,
        g["pos"],
        g["vel"],
        g["pos"],
        g["vel"],
        g["srp"],
        getattr(rec.config.waveform, "reference_range_m", None),  # pulsed: no LO
    )
    scene, dwell = _strip_scene(rec, m, g, frame)
    return [ch], scene, dwell, "STRIPMAP", sorted(rec.channels)


def _spot_collection(rec, geometry, frame: LocalFrame):
    """(channels, SceneCoordinates, Dwell, mode, left out) of a spotlight recording: the main
    channel on the arc and, when recorded, the bistatic receiver as its own channel."""
    cfg = rec.config
    if rec.pulses != geometry.pulses:
        raise ValueError(
            f"{rec.path}: {rec.pulses} shots recorded, the spotlight geometry plans "
            f"{geometry.pulses}"
        )
    time_s = np.asarray(rec.time_s, np.float64)
    pos, vel = spot_station_local(geometry, time_s)
    srp = np.zeros(3)
    wf = cfg.waveform
    main_ref = geometry.lo_range_m(wf, "main")
    chans = [
        ExportChannel(
            CHANNEL, "main", rec.shots, fx_mapping(cfg), pos, vel, pos, vel, srp, main_ref
        )
    ]
    left_out = []
    for name in sorted(rec.channels):
        if name != "bistatic" or not geometry.bistatic:
            left_out.append(name)
            continue
        lo = geometry.lo_range_m(wf, name)
        rcv = np.broadcast_to(spot_to_local_m(geometry.receiver_m()), pos.shape)
        chans.append(
            ExportChannel(
                f"rtsar-{name}",
                name,
                rec.channels[name],
                fx_mapping(channel_config(cfg, lo)),
                pos,
                vel,
                np.array(rcv),
                np.zeros_like(vel),
                srp,
                lo,
            )
        )
    # The image area: a square about the SRP enclosing the default PFA image (rtsar.spot.pfa).
    plan = PolarFormatPlan(cfg, geometry)
    half = float(np.hypot(np.abs(plan.x_m).max(), np.abs(plan.y_m).max()))
    corners = np.array([[-half, half, 0.0], [half, half, 0.0], [half, -half, 0.0]])
    corners = np.vstack([corners, [[-half, -half, 0.0]]])  # clockwise seen from above
    scene = {
        "EarthModel": "WGS_84",
        "IARP": {
            "ECF": frame.to_ecf(srp),
            "LLH": skwgs84.cartesian_to_geodetic(frame.to_ecf(srp)),
        },
        # The collection plane: IAX = spotlight x (cross-range, east), IAY = spotlight y
        # (down-range), so image coordinates are the spotlight frame's.
        "ReferenceSurface": {
            "Planar": {
                "uIAX": frame.vectors_to_ecf(spot_to_local_m([1.0, 0.0, 0.0])),
                "uIAY": frame.vectors_to_ecf(spot_to_local_m([0.0, 1.0, 0.0])),
            }
        },
        "ImageArea": {"X1Y1": [-half, -half], "X2Y2": [half, half]},
        "ImageAreaCornerPoints": skwgs84.cartesian_to_geodetic(
            frame.to_ecf(spot_to_local_m(corners))
        )[:, :2],
    }
    # Every image point is seen over the whole collection: one COD time (mid-collection, +
    # the SRP's one-way delay as for the strip map) and one dwell, the collection's length.
    t_cod = 0.5 * (time_s[0] + time_s[-1]) + geometry.range_m / C_M_PER_S
    dwell = (np.array([[t_cod]]), np.array([[float(time_s[-1] - time_s[0])]]))
    return chans, scene, dwell, "SPOTLIGHT", left_out


def _pvps(rec, ch: ExportChannel, frame: LocalFrame, dtype, dtau: np.ndarray) -> np.ndarray:
    m = ch.mapping
    pv = np.zeros(rec.pulses, dtype)
    tx = np.asarray(rec.time_s, np.float64)
    srp = frame.to_ecf(ch.srp_m)
    pv["TxPos"], pv["RcvPos"] = frame.to_ecf(ch.tx_m), frame.to_ecf(ch.rcv_m)
    pv["TxVel"], pv["RcvVel"] = frame.vectors_to_ecf(ch.tx_vel), frame.vectors_to_ecf(ch.rcv_vel)
    pv["SRPPos"] = srp
    r_tx = np.linalg.norm(pv["TxPos"] - srp, axis=-1)
    r_rcv = np.linalg.norm(pv["RcvPos"] - srp, axis=-1)
    pv["TxTime"], pv["RcvTime"] = tx, tx + (r_tx + r_rcv) / C_M_PER_S
    u_tx = (pv["TxPos"] - srp) / r_tx[:, None]
    u_rcv = (pv["RcvPos"] - srp) / r_rcv[:, None]
    # CPHD 1.0.1 §6.3: aFDOP = -(Ṙ_tx + Ṙ_rcv)/c (monostatic: -2 Ṙ/c)
    pv["aFDOP"] = -(np.sum(pv["TxVel"] * u_tx, -1) + np.sum(pv["RcvVel"] * u_rcv, -1)) / C_M_PER_S
    wf = rec.config.waveform
    afrr2 = 2.0 / (C_M_PER_S * wf.chirp_rate_hz_per_s)
    pv["aFRR2"], pv["aFRR1"] = afrr2, m.fxc_hz * afrr2
    pv["FX1"], pv["FX2"] = m.fx1_hz, m.fx2_hz
    pv["TOA1"], pv["TOA2"] = m.toa1_s - dtau, m.toa2_s - dtau  # the range window, per vector
    pv["TDTropoSRP"] = 0.0
    pv["SC0"], pv["SCSS"] = m.sc0_hz, m.scss_hz
    pv[ADDED_PVP[0]] = np.asarray(rec.pulse_index, np.int64)
    return pv


def _strip_scene(rec, m, g: dict, frame: LocalFrame):
    """SceneCoordinates and (COD, dwell) polynomials of a strip-map recording."""
    geo, proc = rec.config.geometry, rec.config.processor
    tx = np.asarray(rec.time_s, np.float64)
    # Scene: a plane at the image's centre; IAX along track, IAY north (away from the platform:
    # IAX × IAY is up), so a scene point at cross-track y has IAY = -(y - y_c).
    n = proc.aperture_pulses
    step = geo.along_track_step_m
    x_first = rec.start_along_track_m + 0.5 * (n - 1) * step  # first and last image line
    x_last = rec.start_along_track_m + (rec.pulses - 1 - 0.5 * (n - 1)) * step
    h = g["height_m"]
    ground = np.sqrt(
        np.maximum(
            np.array([m.srp_range_m + 0.5 * C_M_PER_S * t for t in (m.toa1_s, m.toa2_s)]) ** 2
            - h**2,
            0.0,
        )
    )
    y_c = float(np.sqrt(m.srp_range_m**2 - h**2))
    x_c = 0.5 * (x_first + x_last)
    iarp = frame.to_ecf([x_c, y_c, 0.0])
    lines, bins = max(rec.pulses - n + 1, 1), proc.range_bins  # rtsar's image: lines × bins
    spacing = float(ground[1] - ground[0]) / max(bins - 1, 1)
    corners_local = [  # clockwise seen from above (east, south, up is a mirror image)
        [x_first, ground[1], 0.0],
        [x_first, ground[0], 0.0],
        [x_last, ground[0], 0.0],
        [x_last, ground[1], 0.0],
    ]
    corners_llh = skwgs84.cartesian_to_geodetic(frame.to_ecf(np.array(corners_local)))
    scene = {
        "EarthModel": "WGS_84",
        "IARP": {"ECF": iarp, "LLH": skwgs84.cartesian_to_geodetic(iarp)},
        "ReferenceSurface": {
            "Planar": {"uIAX": frame.axes[0], "uIAY": -frame.axes[1]},
        },
        "ImageArea": {
            "X1Y1": [x_first - x_c, y_c - ground[1]],
            "X2Y2": [x_last - x_c, y_c - ground[0]],
        },
        "ImageAreaCornerPoints": corners_llh[:, :2],
        "ImageGrid": {
            "Identifier": "rtsar-image",
            "IARPLocation": [0.5 * (lines - 1), (ground[1] - y_c) / spacing],
            "IAXExtent": {"LineSpacing": step, "FirstLine": 0, "NumLines": lines},
            "IAYExtent": {"SampleSpacing": spacing, "FirstSample": 0, "NumSamples": bins},
        },
    }
    # Centre of aperture of an image point at IAX: when the platform is abeam of it (+ the
    # SRP's one-way delay, the reference time of sarkit's t_ref); the dwell spans the aperture.
    speed = geo.speed_mps
    t_abeam = float(tx[0]) + (x_c - rec.start_along_track_m) / speed + m.srp_range_m / C_M_PER_S
    return scene, (np.array([[t_abeam], [1.0 / speed]]), np.array([[(n - 1) / geo.prf_hz]]))


def build_xml(rec, chans, scene: dict, dwell, mode: str, frame, core_name: str, dtaus):
    """The CPHD XML (without ReferenceGeometry) of a recording's channels."""
    cfg = rec.config
    root = etree.Element(f"{{{CPHD_NS}}}CPHD", nsmap={None: CPHD_NS})
    ew = skcphd.ElementWrapper(root)
    tx = np.asarray(rec.time_s, np.float64)
    start = datetime.datetime(2000, 1, 1)  # rtsar's times are relative: an arbitrary epoch
    ew["CollectionID"] = {
        "CollectorName": "rtsar",
        "CoreName": core_name,
        "CollectType": "MONOSTATIC",  # the reference channel's; a bistatic one has its PVPs
        "RadarMode": {"ModeType": mode},
        "Classification": "UNCLASSIFIED",
        "ReleaseInfo": "UNRESTRICTED",
    }
    # per vector: the SRP's delay varies
    spans = [
        (c.mapping.toa1_s - d, c.mapping.toa2_s - d) for c, d in zip(chans, dtaus, strict=True)
    ]
    tau_span = (min(float(a.min()) for a, _ in spans), max(float(b.max()) for _, b in spans))
    fx_lo = min(c.mapping.fx1_hz for c in chans)
    fx_hi = max(c.mapping.fx2_hz for c in chans)
    ew["Global"] = {
        "DomainType": "FX",
        "SGN": -1,
        "Timeline": {
            "CollectionStart": start,
            "TxTime1": float(tx[0]),
            "TxTime2": float(tx[-1]),
        },
        "FxBand": {"FxMin": fx_lo, "FxMax": fx_hi},
        "TOASwath": {"TOAMin": tau_span[0], "TOAMax": tau_span[1]},
    }
    ew["SceneCoordinates"] = scene
    words = sum(w for _, w, _ in PVP_LAYOUT) + ADDED_PVP[1]
    ew["Data"] = {
        "SignalArrayFormat": "CF8",
        "NumBytesPVP": 8 * words,
        "NumCPHDChannels": len(chans),
        "Channel": [
            {
                "Identifier": c.identifier,
                "NumVectors": rec.pulses,
                "NumSamples": c.mapping.num_samples,
                "SignalArrayByteOffset": sum(
                    rec.pulses * b.mapping.num_samples * 8 for b in chans[:i]
                ),
                "PVPArrayByteOffset": i * rec.pulses * 8 * words,
            }
            for i, c in enumerate(chans)
        ],
        "NumSupportArrays": 0,
    }
    ew["Channel"] = {
        "RefChId": chans[0].identifier,
        "FXFixedCPHD": len({(c.mapping.fx1_hz, c.mapping.fx2_hz) for c in chans}) == 1,
        "TOAFixedCPHD": rec.pulses == 1,
        "SRPFixedCPHD": True,
        "Parameters": [
            {
                "Identifier": c.identifier,
                "RefVectorIndex": rec.pulses // 2,
                "FXFixed": True,
                "TOAFixed": rec.pulses == 1,
                "SRPFixed": True,
                "Polarization": {"TxPol": "UNSPECIFIED", "RcvPol": "UNSPECIFIED"},
                "FxC": c.mapping.fxc_hz,
                "FxBW": c.mapping.fx2_hz - c.mapping.fx1_hz,
                "TOASaved": float(b.max() - a.min()),
                "DwellTimes": {"CODId": "cod", "DwellId": "dwell"},
            }
            for c, (a, b) in zip(chans, spans, strict=True)
        ],
    }
    offset, pvp = 0, {}
    for name, size, fmt in PVP_LAYOUT:
        pvp[name] = {
            "Offset": offset,
            "Size": size,
            "dtype": skcphd.binary_format_string_to_dtype(fmt),
        }
        offset += size
    ew["PVP"] = pvp
    ew["PVP"]["AddedPVP"] = [
        {
            "Name": ADDED_PVP[0],
            "Offset": offset,
            "Size": ADDED_PVP[1],
            "dtype": skcphd.binary_format_string_to_dtype(ADDED_PVP[2]),
        }
    ]
    ew["Dwell"] = {
        "NumCODTimes": 1,
        "CODTime": [{"Identifier": "cod", "CODTimePoly": dwell[0]}],
        "NumDwellTimes": 1,
        "DwellTime": [{"Identifier": "dwell", "DwellTimePoly": dwell[1]}],
    }
    info = etree.SubElement(root, f"{{{CPHD_NS}}}ProductInfo")
    creation = etree.SubElement(info, f"{{{CPHD_NS}}}CreationInfo")
    etree.SubElement(creation, f"{{{CPHD_NS}}}Application").text = f"rtsar {__version__}"
    etree.SubElement(creation, f"{{{CPHD_NS}}}DateTime").text = datetime.datetime.now(
        datetime.timezone.utc
    ).strftime("%Y-%m-%dT%H:%M:%SZ")
    channels = {
        c.identifier: {"name": c.name, "reference_range_m": c.reference_range_m} for c in chans
    }
    for name, value in (
        ("rtsar:config", json.dumps(cfg.to_dict())),
        ("rtsar:scene", json.dumps(rec.scene or {})),
        ("rtsar:start_along_track_m", repr(float(rec.start_along_track_m))),
        ("rtsar:origin_lat_lon_deg", f"{frame.lat_deg!r},{frame.lon_deg!r}"),
        ("rtsar:heading_deg", repr(float(frame.heading_deg))),
        (SPOT_CHANNELS_PARAMETER, json.dumps(channels)),
    ):
        etree.SubElement(info, f"{{{CPHD_NS}}}Parameter", name=name).text = value
    return etree.ElementTree(root)


def write_cphd(rec, path: str | Path, frame: LocalFrame | None = None) -> dict:
    """Write recording ``rec`` (rtsar.sinks.io.Recording) as CPHD 1.0.1 to ``path``; returns
    a summary (vectors, samples, domain, channels written, auxiliary channels left out)."""
    require_formats(skcphd, "CPHD export")
    frame = frame or LocalFrame()
    if rec.pulses < 1:
        raise ValueError(f"{rec.path}: no shots to export")
    spot = spot_geometry_of(rec.scene, rec.path)
    if spot is not None:
        chans, scene, dwell, mode, left_out = _spot_collection(rec, spot, frame)
    else:
        chans, scene, dwell, mode, left_out = _strip_collection(rec, frame)
    dtaus = [c.dtau_s(frame) for c in chans]
    tree = build_xml(rec, chans, scene, dwell, mode, frame, Path(path).stem, dtaus)
    dtype = skcphd.get_pvp_dtype(tree)
    pvps = [_pvps(rec, c, frame, dtype, d) for c, d in zip(chans, dtaus, strict=True)]
    for c, p, d in zip(chans, pvps, dtaus, strict=True):
        if not np.array_equal(srp_delay_s(p, c.mapping.srp_range_m), d):
            raise RuntimeError("CPHD export: the stored PVPs do not reproduce the SRP delays")
    root = tree.getroot()
    root.append(skcphd.compute_reference_geometry(tree, pvps[0]))
    # ReferenceGeometry's place in the schema's sequence: before SupportArray/…/ProductInfo.
    info = root.find(f"{{{CPHD_NS}}}ProductInfo")
    root.remove(info)
    root.append(info)
    meta = skcphd.Metadata(xmltree=tree)
    # Written beside ``path`` and renamed when complete: a run that dies leaves no partial CPHD.
    with replace_when_complete(path) as tmp, open(tmp, "wb") as f, skcphd.Writer(f, meta) as w:
        for c, p, d in zip(chans, pvps, dtaus, strict=True):
            m = c.mapping
            signal = np.empty((rec.pulses, m.num_samples), np.complex64)
            for i in range(0, rec.pulses, 1024):
                signal[i : i + 1024] = shots_to_fx(m, c.shots[i : i + 1024], d[i : i + 1024])
            w.write_signal(c.identifier, signal)
            w.write_pvp(c.identifier, p)
    return {
        "vectors": rec.pulses,
        "samples": chans[0].mapping.num_samples,
        "domain": "FX",
        "mode": mode.lower(),
        "channels": [c.name for c in chans],
        "left_out": left_out,
    }
